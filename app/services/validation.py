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

The execution machinery (chunks, threads, worker processes, Dask, the garbage collector kept
off the heap) is :mod:`railval.app.services.validation_exec`; the cache keys and seal checks
made from the signal rows are :mod:`railval.app.services.validation_rows`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sqlalchemy.orm import Session

from railval.app.services.validation_exec import (
    heap_frozen,
    process_chunks,
    read_and_process,
    source_chunks,
)
from railval.app.services.validation_rows import (
    SameRows,
    SealCheck,
    check_row_seals,
    keys_from_rows,
    source_cache_keys,
)
from railval.core import lazy
from railval.core.errors import InvalidParameter
from railval.core.processing import DEFAULT_ORDER, check_order
from railval.core.stages import current as current_stages
from railval.core.stages import stage
from railval.core.types import SectionInfo
from railval.db import repo

if TYPE_CHECKING:
    from railval.core.validation import ValidationResult

# the EN 14363 processing and the verdict load numba and scipy.signal: imported when the first
# section is processed, so that an unknown campaign or configuration is answered at once
en14363 = lazy.module("railval.core.en14363")
unpack_values = lazy.function("railval.core.en14363", "unpack_values")
source_warnings = lazy.function("railval.core.validation", "source_warnings")
validate = lazy.function("railval.core.validation", "validate")

#: share of the chunks of a run on worker processes collected before the seal check and the
#: first verdict (:class:`_Collector`)
_SEAL_HOLD = 0.8


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
        done = read_and_process(session, camp, [(source, missing)], by_id, order,
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
    #: signal rows with their seals for the full seal check (None: it reads them;
    #: :class:`railval.app.services.validation_rows.SealCheck`)
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
    :class:`SealCheck` before the first verdict)."""
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
    is walked before the workers start; :class:`SealCheck` reads and checks the seals
    while they process)."""
    rows = repo.hash_rows_many(session, camp, [r.id for r in refs])
    return keys_from_rows(rows, [(None, None), *((r.name, r.id) for r in refs)], sections,
                           order), rows


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
        #: chunks (:class:`SealCheck`), only the others are read from the database; the
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
    :class:`SealCheck`), result cache, EN chain, :func:`_verdict` — with the sections
    not in the cache processed in chunks of at most ``chunk_sections`` sections of one
    source (:func:`source_chunks`, the measurement first) by ``workers`` processes (each opens its
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
    with heap_frozen():
        return _validate_configurations(database, campaign_name, configs, order, n_boot, seed,
                                        workers, chunk_sections, scheduler, progress,
                                        check_seals, backend)


def _validate_configurations(database, campaign_name, configs, order, n_boot, seed, workers,
                             chunk_sections, scheduler, progress, check_seals,
                             backend) -> dict[str, ValidationResult]:
    """:func:`validate_configurations` with its arguments checked and the heap frozen."""
    plan = _plan(database, campaign_name, configs, order)
    chunks = source_chunks(plan.todo, chunk_sections)
    # the process workers' chunks do not wait for this process: it may hold the verdicts
    # (and the seal check) until most chunks are in; the threads back end reads the blobs
    # here, between the verdicts, so it checks at the first verdict
    hold = _SEAL_HOLD if backend == "processes" and workers > 1 and scheduler is None else 0.0
    collector = _Collector(plan, order, n_boot, seed, progress,
                           SealCheck(database, plan) if check_seals else None,
                           len(chunks), hold)
    process_chunks(database, plan, chunks, order, workers, scheduler, collector, backend)
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


def validate_configuration(session: Session, campaign_name: repo.CampaignArg,
                           config: repo.ConfigArg, *,
                           order: int = DEFAULT_ORDER, n_boot: int = 1000,
                           seed: int = 0, check_seals: bool = True) -> ValidationResult:
    """Validate configuration ``config`` of ``campaign_name`` against the measurement.

    ``campaign_name``/``config``: the names (resolved here, once) or the references of an
    entrance that resolved them (:func:`railval.db.repo.resolve`; no further lookup).
    ``order``: Butterworth prototype order of both filters; ``n_boot``/``seed``: bootstrap of
    the normalised values. The result's ``info`` records how many sections of each side
    came from the cache. Both sides' signal rows (content hashes and seals, no blob) are
    read first, by two queries (:func:`railval.db.repo.seal_rows_many`); the cache keys
    come from them and are looked up at once; the sections of both sides not in the cache
    are read, decoded and processed as one pipeline (:func:`read_and_process`, the
    measurement's chunks first), every blob row read checked against those rows
    (:class:`SameRows`). The seals of both sides' signals are checked on the same rows
    (as :func:`railval.db.repo.require_sealed` without blobs checks them) before the
    verdict, while the sections are processed: a signal changed outside railval raises
    :class:`railval.db.integrity.IntegrityError` instead of giving a verdict (and nothing
    is cached). Raises :class:`railval.core.errors.NotFound` for unknown names. The heap
    alive on entry is left out of the garbage collector's passes meanwhile
    (:func:`heap_frozen`: a full pass over a server's heap took ≈ 0.1 s).
    """
    check_order(order)
    with heap_frozen():
        return _validate_configuration(session, campaign_name, config, order, n_boot, seed,
                                       check_seals)


def _validate_configuration(session: Session, campaign_name: repo.CampaignArg,
                            config: repo.ConfigArg, order: int,
                            n_boot: int, seed: int, check_seals: bool) -> ValidationResult:
    """:func:`validate_configuration` with the order checked and the heap frozen."""
    with stage("database"):
        camp, conf = repo.resolve(session, campaign_name, config)
        sections = repo.section_infos(session, camp)
        # both sources' signal rows (content hashes and seals, no blob) read once: the cache
        # keys come from them now, the seals are checked on them while the sections are
        # processed, and the blobs read later must carry the same hashes (SameRows)
        rows = repo.seal_rows_many(session, camp, [conf.id])
        keys = keys_from_rows(rows, [(None, None), (conf.name, conf.id)], sections, order)
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
            later["provenance"] = calibration_provenance(session, camp, conf)
            if check_seals:
                check_row_seals(session, camp, conf, rows)

    if todo[None] or todo[conf.name]:
        # one pipeline over both sources (the measurement first): its last chunks overlap
        # the configuration's first; the seals are checked while the chunks are processed
        by_id = {s.id: s for s in sections}
        done = read_and_process(session, camp, [(src, todo[name]) for src, name in
                                                 ((None, None), (conf, conf.name))
                                                 if todo[name]],
                                 by_id, order, meanwhile, SameRows(camp, conf, rows))
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
