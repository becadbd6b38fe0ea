"""railval.app.services.validation on SQLite and PostgreSQL (``database`` fixture): result equals the
in-memory path, and the result cache spares the processing — counted, not timed."""

from __future__ import annotations

import json

import pytest

from railval.app.services import validation as service
from railval.app.services import validation_exec
from railval.core import en14363
from railval.core.en14363 import section_cache_key
from railval.core.errors import NotFound
from railval.core.validation import validate_signalsets
from railval.db import repo
from railval.db.importer import import_campaign
from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("campaign")
    write_demo_campaign(folder, n_configs=2, fs=200.0)
    return folder


@pytest.fixture
def counting(monkeypatch):
    """Count the sections processed by en14363.evaluate_batch and the blob reads."""
    counts = {"processed": 0, "loads": 0}
    # every blob read goes through repo.fetch_signalsets (load_signalsets calls it too)
    real_eval, real_load = en14363.evaluate_batch, repo.fetch_signalsets

    def eval_batch(sets, secs, **kw):
        counts["processed"] += len(sets)
        return real_eval(sets, secs, **kw)

    def load(*a, **kw):
        counts["loads"] += 1
        return real_load(*a, **kw)

    monkeypatch.setattr(en14363, "evaluate_batch", eval_batch)
    monkeypatch.setattr(repo, "fetch_signalsets", load)
    return counts


def test_validate_configuration_and_cache(database, campaign_folder, counting):
    import_campaign(database, campaign_folder)
    reads = -(-12 // validation_exec.PIPELINE_CHUNK)  # blob queries per source of 12 sections
    with database.write_session(deferred=True) as s:
        first = service.validate_configuration(s, "demo", "baseline", n_boot=200)
    assert counting == {"processed": 24, "loads": 2 * reads}  # 12 measured + 12 simulated
    assert first.info["sections_measured"] == {"cached": 0, "computed": 12}
    doc = first.to_dict()
    json.dumps(doc, allow_nan=False)
    assert doc["coverage"]["ok"] and doc["coverage"]["sections"] == 12

    with database.write_session(deferred=True) as s:
        again = service.validate_configuration(s, "demo", "baseline", n_boot=200)
    # nothing processed, no blob read: both sides came from the cache
    assert counting == {"processed": 24, "loads": 2 * reads}
    assert again.info["sections_simulated"] == {"cached": 12, "computed": 0}
    strip = lambda d: {k: v for k, v in d.items() if k != "info"}
    assert strip(again.to_dict()) == strip(doc)

    with database.write_session(deferred=True) as s:
        other = service.validate_configuration(s, "demo", "variant1", n_boot=200)
    # a new configuration costs only its own 12 sections; the measured side is cached
    assert counting == {"processed": 36, "loads": 3 * reads}
    assert other.info["sections_measured"] == {"cached": 12, "computed": 0}

    with database.write_session(deferred=True) as s:
        service.validate_configuration(s, "demo", "variant1", n_boot=0, order=2)
    assert counting["processed"] == 60  # another filter order is another key


def test_service_equals_in_memory_path(database, campaign_folder):
    import_campaign(database, campaign_folder)
    with database.write_session(deferred=True) as s:
        db_result = service.validate_configuration(s, "demo", "baseline", n_boot=100, seed=3)
        sections = repo.section_infos(s, "demo")
        vehicle = repo.vehicle_info(s, "demo")
        measured = repo.load_signalsets(s, "demo", None)
        simulated = repo.load_signalsets(s, "demo", "baseline")
    mem = validate_signalsets(measured, simulated, sections, vehicle, n_boot=100, seed=3)
    a, b = db_result.to_dict(), mem.to_dict()
    a.pop("info")
    assert a == b
    assert db_result.pairs.equals(mem.pairs)


def test_cache_key_changes_with_content_and_range():
    from railval.core.types import SectionInfo

    sec = SectionInfo("S1", 0, 0, 100, 1, 10.0, 90.0)
    base = section_cache_key(sec, 200.0, 1000, "d" * 64, {"Y_w1L": "a", "Q_w1L": "b"}, 4)
    assert base == section_cache_key(sec, 200.0, 1000, "d" * 64,
                                     {"Q_w1L": "b", "Y_w1L": "a"}, 4)
    variants = [
        section_cache_key(sec, 200.0, 1000, "d" * 64, {"Y_w1L": "c", "Q_w1L": "b"}, 4),
        section_cache_key(sec, 200.0, 1000, "e" * 64, {"Y_w1L": "a", "Q_w1L": "b"}, 4),
        section_cache_key(SectionInfo("S1", 0, 0, 100, 1, 10.0, 91.0), 200.0, 1000,
                          "d" * 64, {"Y_w1L": "a", "Q_w1L": "b"}, 4),
        section_cache_key(sec, 200.0, 1000, "d" * 64, {"Y_w1L": "a", "Q_w1L": "b"}, 6),
        section_cache_key(sec, 250.0, 1000, "d" * 64, {"Y_w1L": "a", "Q_w1L": "b"}, 4),
    ]
    assert len({base, *variants}) == 6


def test_unknown_names(sqlite_database, campaign_folder):
    import_campaign(sqlite_database, campaign_folder)
    with sqlite_database.write_session(deferred=True) as s:
        with pytest.raises(NotFound, match="configuration 'nope' not found"):
            service.validate_configuration(s, "demo", "nope")
        with pytest.raises(NotFound, match="campaign 'x' not found"):
            service.validate_configuration(s, "x", "baseline")


@pytest.mark.parametrize("workers", [1, 2])
def test_validate_configurations_equals_single(sqlite_database, tmp_path, workers):
    write_demo_campaign(tmp_path / "c", n_configs=2, fs=200.0)
    import_campaign(sqlite_database, tmp_path / "c")
    many = service.validate_configurations(sqlite_database, "demo", n_boot=50, workers=workers,
                                           chunk_sections=5)
    assert list(many) == ["baseline", "variant1"]
    for name, res in many.items():
        with sqlite_database.write_session(deferred=True) as s:
            single = service.validate_configuration(s, "demo", name, n_boot=50)
        # the single call found every section in the cache the batch call wrote
        assert single.info["sections_measured"] == {"cached": 12, "computed": 0}
        assert single.info["sections_simulated"] == {"cached": 12, "computed": 0}
        a, b = res.to_dict(), single.to_dict()
        a.pop("info"), b.pop("info")
        assert a == b
