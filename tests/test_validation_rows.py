"""One validation reads its signal rows (content hashes and seals) once: the result-cache
keys come from them exactly as :func:`source_cache_keys` makes them, the seals are checked
on them, and blobs read later that do not match them are refused (nothing cached)."""

from __future__ import annotations

import pytest
from sqlalchemy import func, select

from railval.app.services import validation as service
from railval.app.services import validation_rows
from railval.db import integrity, repo
from railval.db.importer import import_campaign
from railval.db.models import ResultCache
from tests.factories import write_demo_campaign


@pytest.fixture()
def demo(database, tmp_path):
    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(database, tmp_path / "c")
    return database


def test_keys_from_the_rows_are_the_source_cache_keys(demo):
    with demo.session() as s:
        camp, conf = repo.resolve(s, "demo", "variant1")
        secs = repo.section_infos(s, camp)
        rows = repo.seal_rows_many(s, camp, [conf.id])
        for order in (4, 5):
            keys = validation_rows.keys_from_rows(rows, [(None, None), (conf.name, conf.id)], secs,
                                           order)
            assert {sid: k for (src, sid), k in keys.items() if src is None} == \
                validation_rows.source_cache_keys(s, camp, None, secs, order=order)
            assert {sid: k for (src, sid), k in keys.items() if src == "variant1"} == \
                validation_rows.source_cache_keys(s, camp, conf, secs, order=order)
            assert len(keys) == 2 * len(secs)


def test_configuration_stored_again_while_validated(demo, monkeypatch):
    """The configuration is stored again (other samples) after its rows were read for the
    keys and before its blobs are read. SQLite: the reading transaction keeps its snapshot,
    so the validation judges the samples it began with and caches them under their keys.
    PostgreSQL (read committed): the blobs read are the new ones, which the keys and the
    checked seals do not name — refused, nothing cached. Either way a second run judges the
    new samples."""
    with demo.write_session(deferred=True) as s:
        service.validate_configuration(s, "demo", "baseline", n_boot=0)  # measurement cached
        cached_before = s.scalar(select(func.count()).select_from(ResultCache))
        camp, _ = repo.resolve(s, "demo", "variant1")
        sets = repo.load_signalsets(s, camp, "variant1")
    for ss in sets.values():
        for name in list(ss.channels):
            ss.channels[name] = ss.channels[name] * 1.01
    real = repo.cache_get_many
    stored = []

    def store_meanwhile(session, keys):
        got = real(session, keys)
        if not stored:
            with demo.session(write=True) as w:
                repo.store_configuration(w, "demo", "variant1", parent=None, effects={},
                                         parameters={}, description="", signalsets=sets,
                                         replace=True)
            stored.append(True)
        return got

    monkeypatch.setattr(service.repo, "cache_get_many", store_meanwhile)
    if demo.engine.dialect.name == "sqlite":
        with demo.write_session(deferred=True) as s:
            old = service.validate_configuration(s, "demo", "variant1", n_boot=0)
        monkeypatch.setattr(service.repo, "cache_get_many", real)
        with demo.write_session(deferred=True) as s:
            again = service.validate_configuration(s, "demo", "variant1", n_boot=0)
            first = service.validate_configuration(s, "demo", "baseline", n_boot=0)
        assert stored and old.info["sections_simulated"]["computed"] == len(sets)
        assert again.info["sections_simulated"]["computed"] == len(sets)  # other keys
        assert old.to_dict()["quantities"] != again.to_dict()["quantities"]
        assert first.info["sections_simulated"]["computed"] == 0
        return
    with pytest.raises(integrity.IntegrityError, match="changed while it was validated"), \
            demo.write_session(deferred=True) as s:
        service.validate_configuration(s, "demo", "variant1", n_boot=0)
    with demo.write_session(deferred=True) as s:
        assert s.scalar(select(func.count()).select_from(ResultCache)) == cached_before
        res = service.validate_configuration(s, "demo", "variant1", n_boot=0)
    assert stored and res.info["sections_simulated"]["computed"] == len(sets)
