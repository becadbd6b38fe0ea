"""The main process's overheads around the EN chain (issue 26): the cache keys of every
source read at once, the seals of many configurations checked from two queries and a
one-shot HMAC. Each is compared with an independent computation: the per-source key path
(:func:`source_cache_keys`), ``hmac.new`` (RFC 2104), and the one-configuration check
(:func:`repo.require_sealed`), and a forged or missing seal is still refused."""

from __future__ import annotations

import hashlib
import hmac

import pytest
from sqlalchemy import select, update

from railval.app.bench import bench_dynotrain as bench
from railval.app.services import validation as V
from railval.app.services import validation_rows
from railval.db import integrity, repo
from railval.db.engine import connect
from railval.db.models import Channel, Configuration, Recording, Section, Signal


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    path = tmp_path_factory.mktemp("ovh")
    bench.build(path, 3, 4, 5000, 200.0)
    db = connect(f"sqlite:///{path / 'dynotrain.db'}")
    yield db
    db.dispose()


def test_one_shot_mac_is_hmac_sha256():
    secret, parts = b"k" * 40, (b"signal2", b"12", b"a\0b", "é".encode())
    want = hmac.new(secret, b"\0".join(parts), hashlib.sha256).digest()
    assert integrity._mac(secret, *parts) == want
    assert integrity._mac(secret + b"x", *parts) != want


def test_plan_keys_equal_the_per_source_keys(tiny):
    with tiny.session() as s:
        camp, _ = repo.resolve(s, "dynotrain-bench")
        secs = repo.section_infos(s, camp)
        refs = [repo.resolve(s, camp, c)[1] for c in ("c002", "c000")]
        keys, (recs, by_rec) = V._plan_keys(s, camp, refs, secs, 4)
        want = {}
        for name, ref in [(None, None), *((r.name, r) for r in refs)]:
            want |= {(name, sid): k for sid, k in
                     validation_rows.source_cache_keys(s, camp, ref, secs, order=4).items()}
    assert keys == want and len(keys) == 3 * 4
    assert list(keys) == list(want)  # measurement first, then the configurations in order
    assert len(recs) == 12 and sum(map(len, by_rec.values())) == 12 * len(bench.CHANNELS)
    assert len(set(keys.values())) == len(keys)  # the sources' samples differ


def test_many_configurations_equal_one_at_a_time(tiny):
    with tiny.session(write=True) as s:
        repo.cache_delete(s, prefix="en14363:")
    many = V.validate_configurations(tiny, "dynotrain-bench", ["c001", "c000"], n_boot=30)
    assert list(many) == ["c001", "c000"]
    for name, res in many.items():
        with tiny.write_session(deferred=True) as s:
            one = V.validate_configuration(s, "dynotrain-bench", name, n_boot=30)
        a, b = res.to_dict(), one.to_dict()
        for d in (a, b):
            d["info"].pop("sections_measured"), d["info"].pop("sections_simulated")
        assert a == b


def _signal(s, section: str, config: str | None, channel: str):
    cond = (Recording.configuration_id.is_(None) if config is None else
            Recording.configuration_id == select(Configuration.id)
            .where(Configuration.name == config).scalar_subquery())
    return s.execute(select(Signal.id, Signal.provenance)
                     .join(Recording, Signal.recording_id == Recording.id)
                     .join(Section, Recording.section_id == Section.id)
                     .join(Channel, Signal.channel_id == Channel.id)
                     .where(Channel.name == channel, Section.section_id == section, cond)
                     ).first()


@pytest.mark.parametrize("config, seal, why", [
    ("c001", "v2:" + "0" * 64, "fails its seal"),
    (None, None, "has no seal"),
])
def test_a_broken_seal_is_refused_with_the_single_check_message(tiny, config, seal, why):
    chan = bench.CHANNELS[0]
    with tiny.session(write=True) as s:
        sid, prov = _signal(s, "S02", config, chan)
        new = {k: v for k, v in prov.items() if k != "seal"}
        if seal is not None:
            new["seal"] = seal
        s.execute(update(Signal).where(Signal.id == sid).values(provenance=new))
    try:
        with tiny.session() as s:
            with pytest.raises(integrity.IntegrityError) as single:
                repo.require_sealed(s, "dynotrain-bench", "c001", blobs=False)
            with pytest.raises(integrity.IntegrityError) as many:
                repo.require_sealed_many(s, "dynotrain-bench", ["c000", "c001"], blobs=False)
            repo.require_sealed_many(s, "dynotrain-bench", ["c002"] if config else [],
                                       blobs=False)
        assert str(many.value) == str(single.value) if config else "'c000'" in str(many.value)
        assert why in str(single.value) and "section S02, " in str(single.value)
        with pytest.raises(integrity.IntegrityError, match=why):
            V.validate_configurations(tiny, "dynotrain-bench", ["c001"], n_boot=0)
    finally:
        with tiny.session(write=True) as s:
            s.execute(update(Signal).where(Signal.id == sid).values(provenance=prov))
    with tiny.session() as s:
        repo.require_sealed_many(s, "dynotrain-bench", ["c000", "c001", "c002"], blobs=False)


def test_values_under_equal_value_under_per_pair(tiny):
    import numpy as np

    from railval.core.definitions import CHOSEN, READINGS
    from railval.core.pairing import gather_pairs, values_under

    plan = V._plan(tiny, "dynotrain-bench", ["c000"], 4)
    m, s = plan.values[None], plan.values["c000"]
    common = sorted(set(m) & set(s))
    pairs = gather_pairs(m, s, {x.id: x for x in plan.sections}, common)
    got = values_under(pairs, s, 3)
    n_alt = 0
    for reading in READINGS:
        if reading == CHOSEN:
            continue
        want = [s[sid].value_under(reading.id, k) for sid, kept, *_ in pairs.by_section
                for k in kept]
        assert got[reading.id].dtype == np.float64
        np.testing.assert_array_equal(got[reading.id], np.array(want, dtype=np.float64))
        n_alt += int(np.sum(got[reading.id] != np.concatenate([r[3] for r in pairs.by_section])))
    assert n_alt > 0  # some reading changes some value: the alternatives were looked up


def test_batched_seal_check_equals_one_at_a_time():
    secret = b"s" * 40
    rec = (17, "d" * 64, 500.0, 0.25, 20000)
    names = ("camp\\x", "S\x0001", "")
    rows, want = [], []
    for k, chan in enumerate(["Y_w1L", "Q\\w1R", "ay\x00cb", "é"]):
        cid, sha = 3 + k, f"{k:064x}"
        v2 = integrity.seal_signal(secret, rec[0], cid, sha, *rec[1:], names=(*names, chan))
        v1 = integrity.seal_signal(secret, rec[0], cid, sha, *rec[1:])
        for seal in (v2, v1, v2[:-1] + "0" if v2[-1] != "0" else v2[:-1] + "1",
                     "v2:" + "f" * 64, v1[::-1]):
            rows.append((chan, cid, sha, seal))
            want.append(integrity.check_signal_seal(secret, seal, rec[0], cid, sha, *rec[1:],
                                                    (*names, chan)))
    got = integrity.check_signal_seals(secret, rec, names, rows)
    assert got == want and want.count(True) == 8 and len(want) == 20
    assert not any(integrity.check_signal_seals(secret, (18, *rec[1:]), names, rows))
    assert not any(integrity.check_signal_seals(secret, rec, ("camp\\x", "S01", ""), rows[::5]))


@pytest.fixture
def imported(database, tmp_path):
    """The tiny bench campaign (measurement + c000) imported into a database of each
    backend: the seal is read by the database's own JSON operator there."""
    from railval.db.importer import import_campaign

    bench.build(tmp_path, 1, 3, 5000, 200.0)
    import_campaign(database, tmp_path / "campaign")
    return database


def test_seal_read_by_the_database_refuses_a_forged_seal_on_every_backend(imported):
    chan = bench.CHANNELS[0]
    with imported.session() as s:
        repo.require_sealed_many(s, "dynotrain-bench", ["c000"], blobs=False)
    with imported.session(write=True) as s:
        sid, prov = _signal(s, "S02", "c000", chan)
        s.execute(update(Signal).where(Signal.id == sid)
                  .values(provenance={**prov, "seal": "v2:" + "0" * 64}))
    with imported.session() as s:
        with pytest.raises(integrity.IntegrityError, match="fails its seal") as single:
            repo.require_sealed(s, "dynotrain-bench", "c000", blobs=False)
        with pytest.raises(integrity.IntegrityError) as many:
            repo.require_sealed_many(s, "dynotrain-bench", ["c000"], blobs=False)
    assert str(many.value) == str(single.value)
    with pytest.raises(integrity.IntegrityError, match="fails its seal"):
        V.validate_configurations(imported, "dynotrain-bench", ["c000"], n_boot=0)
