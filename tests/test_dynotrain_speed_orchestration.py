"""Orchestration of :func:`railval.app.services.validation.validate_configurations`: the
threads back end and the process pool give the same verdicts as one configuration at a time;
chunks are near-equal and start with the measurement; every configuration is judged once,
as soon as its values are complete; row threads follow :func:`railval.core.workers.row_threads`."""

from __future__ import annotations

import threading

import pytest

from railval.app.services import validation as service
from railval.app.services.validation_exec import source_chunks
from railval.core import workers
from railval.core.errors import InvalidParameter
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign


def test_chunks_are_near_equal_and_measurement_first():
    todo = {"a": [f"S{i}" for i in range(17)], None: [f"S{i}" for i in range(12)]}
    chunks = source_chunks(todo, 8)
    assert [c[0] for c in chunks] == [None, None, "a", "a", "a"]
    assert [len(c[1]) for c in chunks] == [6, 6, 5, 6, 6]
    assert [s for c in chunks if c[0] == "a" for s in c[1]] == todo["a"]
    assert source_chunks({"a": ["S1"]}, 8) == [("a", ["S1"])]
    assert source_chunks({}, 8) == []


def test_row_threads_override_is_per_context():
    base = workers.thread_count()
    seen = []
    with workers.row_threads(1):
        assert workers.thread_count() == 1
        t = threading.Thread(target=lambda: seen.append(workers.thread_count()))
        t.start()
        t.join()
    assert workers.thread_count() == base
    assert seen == [base]  # a plain thread does not inherit the context


@pytest.mark.parametrize("backend", ["threads", "processes"])
def test_backends_equal_single_validation(sqlite_database, tmp_path, backend, monkeypatch):
    write_demo_campaign(tmp_path / "c", n_configs=3, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    judged = []
    real = service._verdict

    def counting(measured, simulated, *a, **kw):
        # judged only once the measurement and this configuration are complete
        assert len(measured) == 12 and len(simulated) == 12
        judged.append(a[-1]["configuration"])
        return real(measured, simulated, *a, **kw)

    monkeypatch.setattr(service, "_verdict", counting)
    many = service.validate_configurations(sqlite_database, "demo", n_boot=50, workers=2,
                                           chunk_sections=5, backend=backend)
    assert sorted(judged) == sorted(many) and len(judged) == len(set(judged)) == 3
    for name, res in many.items():
        with sqlite_database.write_session(deferred=True) as s:
            single = service.validate_configuration(s, "demo", name, n_boot=50)
        assert single.info["sections_simulated"] == {"cached": 12, "computed": 0}
        a, b = res.to_dict(), single.to_dict()
        assert a.pop("info")["sections_simulated"] == {"cached": 0, "computed": 12}
        b.pop("info")
        assert a == b
        assert res.pairs.equals(single.pairs)
    # everything cached now: judged from the cache alone
    again = service.validate_configurations(sqlite_database, "demo", n_boot=50, workers=2,
                                            backend=backend)
    assert {k: v.to_dict()["quantities"] for k, v in again.items()} == \
        {k: v.to_dict()["quantities"] for k, v in many.items()}


def test_unknown_backend_is_refused(sqlite_database):
    with pytest.raises(InvalidParameter, match="backend"):
        service.validate_configurations(sqlite_database, "demo", backend="fibres")


@pytest.mark.parametrize("backend", ["threads", "processes"])
def test_forged_configuration_signal_refused_before_any_verdict(sqlite_database, tmp_path,
                                                                backend, monkeypatch):
    """The seals are checked while the chunks are processed: a forged signal of the second
    configuration still raises before any verdict, and nothing is written to the cache."""
    from sqlalchemy import func, select, update

    from railval.db import codec, integrity
    from railval.db.models import ResultCache, Signal

    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    with sqlite_database.session(write=True) as s:
        sig_id, blob, _prov = _variant1_signal(s, "S05", "Q_w2R")
        forged, sha = codec.encode(codec.decode(blob) + 1.0)
        s.execute(update(Signal).where(Signal.id == sig_id).values(blob=forged, sha256=sha))
    judged = []
    monkeypatch.setattr(service, "_verdict", lambda *a, **kw: judged.append(a) or None)
    with pytest.raises(integrity.IntegrityError,
                       match="stored signals of 'variant1'.*section S05, configuration 'variant1', "
                             "Q_w2R"):
        service.validate_configurations(sqlite_database, "demo", n_boot=0, workers=2,
                                        chunk_sections=4, backend=backend)
    assert judged == []
    with sqlite_database.session() as s:
        assert s.scalar(select(func.count()).select_from(ResultCache)) == 0


def test_single_validation_checks_seals_while_processing_and_caches_nothing(sqlite_database,
                                                                              tmp_path):
    """validate_configuration checks the seals while the configuration's sections are
    processed (the measurement cached): a forged signal raises and leaves no cache entry of
    the configuration; intact, the same call gives the verdict."""
    from sqlalchemy import func, select, update

    from railval.db import codec, integrity
    from railval.db.models import ResultCache, Signal

    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    with sqlite_database.write_session(deferred=True) as s:
        service.validate_configuration(s, "demo", "baseline", n_boot=0)
    with sqlite_database.session() as s:
        cached_before = s.scalar(select(func.count()).select_from(ResultCache))
    assert cached_before == 24
    with sqlite_database.session(write=True) as s:
        sig_id, blob, _prov = _variant1_signal(s, "S02", "Y_w1L")
        forged, sha = codec.encode(codec.decode(blob) * 0.9)
        s.execute(update(Signal).where(Signal.id == sig_id).values(blob=forged, sha256=sha))
    with pytest.raises(integrity.IntegrityError,
                       match="section S02, configuration 'variant1', Y_w1L: fails its seal"), \
            sqlite_database.write_session(deferred=True) as s:
        service.validate_configuration(s, "demo", "variant1", n_boot=0)
    with sqlite_database.write_session(deferred=True) as s:
        assert s.scalar(select(func.count()).select_from(ResultCache)) == cached_before
        res = service.validate_configuration(s, "demo", "baseline", n_boot=0)
    assert res.info["sections_simulated"] == {"cached": 12, "computed": 0}


@pytest.mark.parametrize("hold", [0.0, 1.0])
def test_forged_seal_read_by_the_workers_is_refused(sqlite_database, tmp_path, hold,
                                                    monkeypatch):
    """The seals the worker processes read with the blobs are checked like those read by
    the main process: a seal forged with the samples (hold 1.0: every source's rows come
    from the chunks; 0.0: most from the database) raises the same error, before any
    verdict, and nothing is cached."""
    from sqlalchemy import func, select, update

    from railval.db import codec, integrity, repo
    from railval.db.models import ResultCache, Signal

    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    with sqlite_database.session(write=True) as s:
        sig_id, blob, prov = _variant1_signal(s, "S02", "Y_w1L")
        forged, sha = codec.encode(codec.decode(blob) * 2.0)
        s.execute(update(Signal).where(Signal.id == sig_id).values(
            blob=forged, sha256=sha, provenance={**prov, "seal": "v2:" + "0" * 64}))
    monkeypatch.setattr(service, "_SEAL_HOLD", hold)
    judged = []
    monkeypatch.setattr(service, "_verdict", lambda *a, **kw: judged.append(a) or None)
    with pytest.raises(integrity.IntegrityError,
                       match=r"stored signals of 'variant1' are not intact \(1 problem\(s\)\): "
                             "section S02, configuration 'variant1', Y_w1L: fails its seal"):
        service.validate_configurations(sqlite_database, "demo", n_boot=0, workers=2,
                                        chunk_sections=4)
    assert judged == []
    with sqlite_database.session() as s:
        assert s.scalar(select(func.count()).select_from(ResultCache)) == 0
    with sqlite_database.session() as s:  # the same message as the full check gives
        with pytest.raises(integrity.IntegrityError, match="fails its seal"):
            names = [c.name for c in repo.list_configurations(s, "demo")]
            repo.require_sealed_many(s, "demo", names, blobs=False)


def _variant1_signal(session, section: str, channel: str):
    """(id, blob, provenance) of a stored signal of configuration variant1 of the demo
    campaign: the signal a forgery test alters."""
    from sqlalchemy import select

    from railval.db.models import Channel, Configuration, Recording, Section, Signal

    return session.execute(
        select(Signal.id, Signal.blob, Signal.provenance)
        .join(Recording, Signal.recording_id == Recording.id)
        .join(Section, Recording.section_id == Section.id)
        .join(Channel, Signal.channel_id == Channel.id)
        .join(Configuration, Recording.configuration_id == Configuration.id)
        .where(Channel.name == channel, Section.section_id == section,
               Configuration.name == "variant1")).first()
