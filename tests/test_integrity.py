"""Forged or damaged evidence never reaches a verdict or a report unnoticed (SQLite and
PostgreSQL): sealed cache entries, sealed signals, a digest over the verdict, `railval verify`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sqlalchemy import select, update

from railval.app.cli import main
from railval.app.services.validation import validate_configuration
from railval.app.services.validation_rows import source_cache_keys
from railval.db import codec, integrity, repo
from railval.db.importer import import_campaign
from railval.db.models import Channel, Recording, ResultCache, Section, Signal
from tests.factories import write_demo_campaign


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("integrity")
    write_demo_campaign(folder, n_sections=12, fmt="parquet", seed=11, name="demo")
    return folder


@pytest.fixture
def db(database, campaign_dir):
    import_campaign(database, campaign_dir)
    return database


def _verdict(db):
    with db.write_session(deferred=True) as s:
        r = validate_configuration(s, "demo", "baseline", n_boot=0)
    return r.validated, json.dumps(r.to_dict()["quantities"], sort_keys=True, default=str)


def test_copied_cache_rows_do_not_change_the_verdict(db):
    honest = _verdict(db)
    assert any(q["mean"] for q in json.loads(honest[1]))  # the simulation differs
    with db.session(write=True) as s:
        secs = repo.section_infos(s, "demo")
        meas = source_cache_keys(s, "demo", None, secs)
        conf = source_cache_keys(s, "demo", "baseline", secs)
        for sid, key in conf.items():  # the probe's attack: measurement values under the
            value = s.scalar(select(ResultCache.value).where(ResultCache.key == meas[sid]))
            s.execute(update(ResultCache).where(ResultCache.key == key).values(value=value))
    assert _verdict(db) == honest
    with db.session() as s:
        doc = repo.verify_storage(s, blobs=False)
    # the copied rows were recomputed and re-sealed by the validation above
    assert doc["ok"], doc


def test_cache_value_written_without_the_secret_is_not_used(db):
    _verdict(db)
    with db.session(write=True) as s:
        key = next(iter(source_cache_keys(s, "demo", "baseline", repo.section_infos(s, "demo")).values()))
        payload = repo.cache_get(s, key)
        assert payload is not None
        s.execute(update(ResultCache).where(ResultCache.key == key).values(value=payload))
    with db.session() as s:
        assert repo.cache_get(s, key) is None
        doc = repo.verify_storage(s, blobs=False)
    assert not doc["ok"] and doc["cache_unauthentic"] == [key]


def _first_signal(s, config_name: str | None):
    q = (select(Signal.id, Signal.blob, Channel.name, Section.section_id)
         .join(Recording, Signal.recording_id == Recording.id)
         .join(Section, Recording.section_id == Section.id)
         .join(Channel, Signal.channel_id == Channel.id)
         .where(Channel.name == "Y_w1L", Section.section_id == "S03"))
    q = q.where(Recording.configuration_id.is_(None)) if config_name is None else q.where(
        Recording.configuration_id.is_not(None))
    return s.execute(q).first()


def test_rescaled_signal_with_recomputed_hash_is_refused(db):
    with db.session(write=True) as s:
        sid_, blob, _, _ = _first_signal(s, "baseline")
        forged, sha = codec.encode(codec.decode(blob) * 0.5)
        s.execute(update(Signal).where(Signal.id == sid_).values(blob=forged, sha256=sha))
    with pytest.raises(integrity.IntegrityError,
                       match="section S03, configuration 'baseline', Y_w1L: fails its seal"):
        _verdict(db)
    with db.session() as s:
        doc = repo.verify_storage(s, blobs=True)
    assert not doc["ok"]
    assert [p["channel"] for p in doc["campaigns"]["demo"]] == ["Y_w1L"]


def test_flipped_byte_is_refused_when_the_evidence_is_read(db):
    with db.session(write=True) as s:
        sid_, blob, _, _ = _first_signal(s, None)
        b = bytearray(blob)
        b[-5] ^= 0x01
        s.execute(update(Signal).where(Signal.id == sid_).values(blob=bytes(b)))
    with db.session() as s:
        problems = repo.verify_seals(s, "demo", "baseline")
        assert [(p["section"], p["configuration"], p["channel"]) for p in problems] == [
            ("S03", None, "Y_w1L")]
        with pytest.raises(integrity.IntegrityError, match="not intact"):
            repo.require_sealed(s, "demo", "baseline")
    # not cached yet: validate decodes the blob and checks it against its hash
    from railval.core.errors import InvalidSignal

    with pytest.raises(InvalidSignal, match="section 'S03', Y_w1L: .*railval verify"):
        _verdict(db)


def test_report_refuses_damaged_evidence_and_digest_covers_the_verdict(db, monkeypatch):
    from railval.app.report import build_report
    from railval.app.state import Backend

    rep = build_report(Backend(db), "demo", "baseline", worst_cases=0)
    backend = Backend(db)
    real = backend.validation

    def flipped(campaign, configuration):
        res = real(campaign, configuration)
        res.validated = not res.validated
        return res

    monkeypatch.setattr(backend, "validation", flipped)
    forged = build_report(backend, "demo", "baseline", worst_cases=0)
    assert forged.validated != rep.validated
    assert forged.digest != rep.digest  # same hashes, different verdict → different digest
    with db.session(write=True) as s:
        sid_, blob, _, _ = _first_signal(s, "baseline")
        b = bytearray(blob)
        b[-9] ^= 0x10
        s.execute(update(Signal).where(Signal.id == sid_).values(blob=bytes(b)))
    with pytest.raises(integrity.IntegrityError, match="stored signals of 'baseline' are not intact"):
        build_report(Backend(db), "demo", "baseline", worst_cases=0)


def test_cli_verify(db, capsys):
    code = main(["--db", db.url, "verify"])
    out = capsys.readouterr().out
    assert code == 0 and "intact" in out
    with db.session(write=True) as s:
        sid_, blob, _, _ = _first_signal(s, "baseline")
        forged, sha = codec.encode(codec.decode(blob) + 1.0)
        s.execute(update(Signal).where(Signal.id == sid_).values(blob=forged, sha256=sha))
    code = main(["--db", db.url, "verify", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 3 and not doc["ok"]
    assert doc["campaigns"]["demo"][0]["error"].startswith("fails its seal")


def test_secret_key_file_is_private(tmp_path):
    from railval.db.engine import connect

    url = f"sqlite:///{tmp_path / 'k.db'}"
    connect(url).init()
    secret = integrity.secret_for(url)
    path = tmp_path / "k.db.key"
    assert path.read_text().strip().encode() == secret
    assert (path.stat().st_mode & 0o777) == 0o600
    assert np.unique(list(secret)).size > 8


def test_signal_seal_binds_names_and_keeps_version_1():
    """Version 2 seals cover campaign, section, configuration and channel names; a version 1
    seal (ids only, written before) is still checked with its own formula."""
    from railval.db.integrity import check_signal_seal, seal_signal

    secret = b"k" * 32
    row = (7, 3, "a" * 64, "b" * 64, 200.0, 0.0, 6000)
    names = ("demo", "S01", "", "Y_w1L")
    v2 = seal_signal(secret, *row, names=names)
    assert v2.startswith("v2:") and check_signal_seal(secret, v2, *row, names)
    for moved in (("other", "S01", "", "Y_w1L"), ("demo", "S02", "", "Y_w1L"),
                  ("demo", "S01", "baseline", "Y_w1L"), ("demo", "S01", "", "Q_w1L"),
                  ("demo", "S0", "1", "Y_w1L")):  # no ambiguity across the separators
        assert not check_signal_seal(secret, v2, *row, moved), moved
    v1 = seal_signal(secret, *row)
    assert not v1.startswith("v2:") and check_signal_seal(secret, v1, *row, ("x", "y", "z", "w"))
    assert not check_signal_seal(b"j" * 32, v2, *row, names)
