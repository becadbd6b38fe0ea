"""Repository API on an imported demo campaign (both backends)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from sqlalchemy import event

from railval.core.errors import InvalidParameter, InvalidSignal, NotFound
from railval.core.types import SignalSet
from railval.db import codec, repo
from railval.db.importer import import_campaign
from railval.db.io import read_table

from tests.factories import CHANNELS, Q0_KN


@pytest.fixture(scope="module")
def shared_demo(module_db_url, demo_campaign_dir):
    """The demo campaign imported once per backend; tests using it must not write."""
    from railval.db.engine import connect

    database = connect(module_db_url)
    database.init()
    import_campaign(database, demo_campaign_dir)
    yield database
    database.dispose()


@pytest.fixture
def demo(shared_demo):
    with shared_demo.session() as s:
        before = repo.row_counts(s)
    yield shared_demo
    with shared_demo.session() as s:
        assert repo.row_counts(s) == before, "a read-only test wrote to the shared database"


@pytest.fixture
def writable_demo(database, demo_campaign_dir):
    import_campaign(database, demo_campaign_dir)
    return database


class QueryCounter:
    def __init__(self, engine):
        self.statements: list[str] = []
        self.engine = engine

    def __enter__(self):
        event.listen(self.engine, "before_cursor_execute", self._on)
        return self

    def __exit__(self, *exc):
        event.remove(self.engine, "before_cursor_execute", self._on)

    def _on(self, conn, cursor, statement, parameters, context, executemany):
        self.statements.append(statement)


def test_campaign_lookup(demo):
    with demo.session() as s:
        c = repo.get_campaign(s, "demo")
        assert repo.get_campaign(s, c.id).name == "demo"
        assert repo.get_campaign(s, str(c.id)) is c
        assert [x.name for x in repo.list_campaigns(s)] == ["demo"]
        with pytest.raises(NotFound, match="'nope' not found; list the campaigns with "
                           "`railval list`") as info:
            repo.get_campaign(s, "nope")
        assert "demo" not in str(info.value)


def test_section_infos_cover_the_four_zones(demo, demo_campaign_dir):
    manifest = json.loads((demo_campaign_dir / "campaign.json").read_text())
    with demo.session() as s:
        infos = repo.section_infos(s, "demo")
    assert [i.id for i in infos] == [x["id"] for x in manifest["sections"]]
    # the factory cycles zones 1, 2, 3, 4 (radii 0, 1200, 500, 300 m, ...), EN 14363 rules
    assert [i.zone for i in infos] == [1, 2, 3, 4] * 3
    s03 = infos[2]
    assert (s03.radius_m, s03.cant_mm, s03.speed_kmh) == (500.0, 130.0, 100.0)
    assert s03.eval_start_m == manifest["sections"][2]["evaluated"]["start_m"]
    assert s03.curve_direction == 1 and infos[1].curve_direction == -1


def test_zone_override_and_boundary(database, demo_campaign_dir, tmp_path):
    folder = tmp_path / "c"
    shutil.copytree(demo_campaign_dir, folder)
    m = json.loads((folder / "campaign.json").read_text())
    m["sections"][0]["zone"] = 2  # straight section forced to zone 2
    m["zone1_min_radius_m"] = 1000  # the 1200 m curve S02 becomes zone 1
    (folder / "campaign.json").write_text(json.dumps(m))
    import_campaign(database, folder)
    with database.session() as s:
        zones = [i.zone for i in repo.section_infos(s, "demo")]
    assert zones[:2] == [2, 1]


def test_vehicle_and_channels(demo):
    with demo.session() as s:
        v = repo.vehicle_info(s, "demo")
        chans = repo.channels(s, "demo")
    assert v["kind"] == "passenger" and v["secondary_suspension"] is True
    assert v["Q0_kN"] == Q0_KN and v["template"] == "coach"
    assert v["parameters"]["m_carbody"] == 32000.0
    assert [c.name for c in chans] == CHANNELS
    assert {c.unit for c in chans if c.kind in ("Y", "Q")} == {"kN"}


def test_load_measured_equals_the_files(demo, demo_campaign_dir):
    manifest = json.loads((demo_campaign_dir / "campaign.json").read_text())
    with demo.session() as s:
        sets = repo.load_signalsets(s, "demo")
    assert sorted(sets) == sorted(x["id"] for x in manifest["sections"])
    for sec in manifest["sections"]:
        table = read_table(demo_campaign_dir / sec["measured"])
        ss = sets[sec["id"]]
        assert ss.fs == 200.0 and len(ss) == table["time_s"].shape[0]
        np.testing.assert_allclose(ss.time_s, table["time_s"], rtol=0, atol=1e-9)
        assert np.array_equal(ss.distance_m, table["distance_m"])
        assert set(ss.channels) == set(CHANNELS)
        for ch in CHANNELS:
            assert np.array_equal(ss.channels[ch], table[ch])
            assert ss.hashes[ch] == codec.content_hash(table[ch])


def test_load_is_one_query_and_filters(demo):
    with demo.session() as s:
        c = repo.get_campaign(s, "demo")
        with QueryCounter(demo.engine) as q:
            sets = repo.load_signalsets(s, c, "variant1", sections=["S02", "S05"],
                                        channels=["Y_w1L", "az_cb_b2"])
        assert len(q.statements) == 1
        # no SQL sort over the blob columns (SQLite would copy every blob into a sorter)
        assert "ORDER BY" not in q.statements[0].upper()
        assert list(sets) == ["S02", "S05"]  # recording order
        assert list(sets["S02"].channels) == ["Y_w1L", "az_cb_b2"]  # channel-name order
        assert list(sets["S02"].hashes) == ["Y_w1L", "az_cb_b2"]
        with QueryCounter(demo.engine) as q:
            hashes = repo.signal_hashes(s, c, "variant1")
        assert len(q.statements) == 1 and "blob" not in q.statements[0]
        assert hashes["S02"]["Y_w1L"] == sets["S02"].hashes["Y_w1L"]
        assert len(hashes) == 12 and all(len(h) == 12 for h in hashes.values())
        measured = repo.signal_hashes(s, c)
        assert measured["S02"]["Y_w1L"] != hashes["S02"]["Y_w1L"]


def test_fetch_reads_now_and_decodes_later_in_another_thread(demo):
    from concurrent.futures import ThreadPoolExecutor

    with demo.session() as s:
        c = repo.get_campaign(s, "demo")
        with QueryCounter(demo.engine) as q:
            decode = repo.fetch_signalsets(s, c, "variant1", sections=["S03", "S01"])
        assert len(q.statements) == 1
        with pytest.raises(NotFound, match="unknown section"):
            repo.fetch_signalsets(s, "demo", sections=["S99"])
        direct = repo.load_signalsets(s, "demo", "variant1", sections=["S03", "S01"])
    with ThreadPoolExecutor(1) as pool:  # session closed: decoding needs no database
        later = pool.submit(decode).result()
    assert list(later) == list(direct) == ["S01", "S03"]
    for sid, ss in direct.items():
        assert later[sid].hashes == ss.hashes and list(later[sid].channels) == sorted(ss.channels)
        assert np.array_equal(later[sid].distance_m, ss.distance_m)
        for ch, values in ss.channels.items():
            assert np.array_equal(later[sid].channels[ch], values)
            assert codec.content_hash(values) == ss.hashes[ch]


def test_load_errors_name_what_is_missing(demo):
    with demo.session() as s:
        with pytest.raises(NotFound, match="configuration 'nope' not found.*baseline, variant1"):
            repo.load_signalsets(s, "demo", "nope")
        with pytest.raises(NotFound, match="unknown section"):
            repo.load_signalsets(s, "demo", sections=["S99"])
        with pytest.raises(NotFound, match="unknown channel"):
            repo.load_signalsets(s, "demo", channels=["Y_w9L"])
        with pytest.raises(NotFound, match="configuration 'nope'"):
            repo.signal_hashes(s, "demo", "nope")


def test_configurations_and_lineage(demo):
    with demo.session() as s:
        assert [c.name for c in repo.list_configurations(s, "demo")] == ["baseline", "variant1"]
        assert [c.name for c in repo.lineage(s, "demo", "variant1")] == ["baseline", "variant1"]
        assert repo.get_configuration(s, "demo", "variant1").parameters["c_yaw_damper"] == pytest.approx(237500.0)
        with pytest.raises(NotFound, match="available: baseline, variant1"):
            repo.get_configuration(s, "demo", "x")


def _scaled(sets: dict[str, SignalSet], gain: float) -> dict[str, SignalSet]:
    return {sid: SignalSet(fs=ss.fs, time_s=ss.time_s.copy(), distance_m=ss.distance_m.copy(),
                           channels={k: v * gain for k, v in ss.channels.items()})
            for sid, ss in sets.items()}


def test_store_configuration_round_trip_and_replace(writable_demo):
    demo = writable_demo
    with demo.session(write=True) as s:
        base = repo.load_signalsets(s, "demo", "baseline", sections=["S01", "S04"])
        new = _scaled(base, 1.01)
        conf = repo.store_configuration(
            s, "demo", "fitted", parent="variant1", effects={"friction_damping": {"mu": 0.3}},
            parameters={"k": 1.0}, description="calibrated", signalsets=new)
        assert new["S01"].hashes["Y_w1L"] == codec.content_hash(new["S01"].channels["Y_w1L"])
        conf_id = conf.id
    with demo.session(write=True) as s:
        assert [c.name for c in repo.lineage(s, "demo", "fitted")] == ["baseline", "variant1", "fitted"]
        got = repo.load_signalsets(s, "demo", "fitted")
        assert sorted(got) == ["S01", "S04"]
        assert np.array_equal(got["S04"].channels["Q_w2R"], new["S04"].channels["Q_w2R"])
        with pytest.raises(InvalidParameter, match="already exists"):
            repo.store_configuration(s, "demo", "fitted", parent=None, effects={}, parameters={},
                                     description="", signalsets=new)
    with demo.session(write=True) as s:
        again = repo.store_configuration(
            s, "demo", "fitted", parent="baseline", effects={}, parameters={"k": 2.0},
            description="refit", signalsets=_scaled(base, 0.99), replace=True)
        assert again.id == conf_id
    with demo.session(write=True) as s:
        got = repo.load_signalsets(s, "demo", "fitted")
        np.testing.assert_allclose(got["S01"].channels["Y_w1L"], base["S01"].channels["Y_w1L"] * 0.99)
        assert [c.name for c in repo.lineage(s, "demo", "fitted")] == ["baseline", "fitted"]
        with pytest.raises(InvalidParameter, match="cycle"):
            repo.store_configuration(s, "demo", "baseline", parent="fitted", effects={},
                                     parameters={}, description="", signalsets=new, replace=True)


def _bad_sets(base: dict[str, SignalSet], case: str) -> dict[str, SignalSet]:
    sets = _scaled(base, 1.0)
    ss = sets["S01"]
    if case == "channel":
        ss.channels["Y_w9L"] = ss.channels["Y_w1L"]
    elif case == "nan":
        ss.channels["Y_w1L"][10] = np.nan
    elif case == "length":
        ss.channels["Y_w1L"] = ss.channels["Y_w1L"][:-1]
    elif case == "distance":
        ss.distance_m[20] = ss.distance_m[19]
    elif case == "fs":
        ss.fs = 100.0
    elif case == "section":
        sets["S99"] = sets.pop("S01")
    return sets


@pytest.mark.parametrize("case,exc,match", [
    ("channel", InvalidSignal, "unknown channel column 'Y_w9L'"),
    ("nan", InvalidSignal, "holds nan at sample 10"),
    ("length", InvalidSignal, r"has \d+ samples, time_s has \d+"),
    ("distance", InvalidSignal, "distance_m is not strictly increasing at sample 20"),
    ("fs", InvalidSignal, "fs is 100.0 Hz but time_s is sampled at 200.0 Hz"),
    ("section", NotFound, "section 'S99' is not in campaign"),
])
def test_store_configuration_rejects_bad_signals(shared_demo, case, exc, match):
    sqlite_database = shared_demo
    with sqlite_database.session() as s:
        base = repo.load_signalsets(s, "demo", "baseline", sections=["S01"])
        before = repo.row_counts(s)
    with pytest.raises(exc, match=match), sqlite_database.session(write=True) as s:
        repo.store_configuration(s, "demo", "bad", parent="baseline", effects={}, parameters={},
                                 description="", signalsets=_bad_sets(base, case))
    with pytest.raises(NotFound, match="parent|'nope'"), sqlite_database.session(write=True) as s:
        repo.store_configuration(s, "demo", "bad", parent="nope", effects={}, parameters={},
                                 description="", signalsets=base)
    with sqlite_database.session() as s:
        assert repo.row_counts(s) == before


def test_result_cache_upsert(database):
    with database.session(write=True) as s:
        assert repo.cache_get(s, "k") is None
        repo.cache_put(s, "k", b"one")
        repo.cache_put(s, "k", b"two")  # same transaction
    with database.session(write=True) as s:
        repo.cache_put(s, "k", b"three")  # new transaction, existing row
        repo.cache_put(s, "other", b"\x00\xff")
    with database.session() as s:
        assert repo.cache_get(s, "k") == b"three"
        assert repo.cache_get(s, "other") == b"\x00\xff"


def test_result_cache_put_many_upserts_in_one_statement(database):
    with database.session(write=True) as s:
        repo.cache_put(s, "a", b"old")
    with database.session(write=True) as s:
        assert repo.cache_get(s, "a") == b"old"  # transaction begun before counting
        with QueryCounter(database.engine) as q:
            repo.cache_put_many(s, {"a": b"new", "b": b"\x01", "c": b""})
            repo.cache_put_many(s, {})
        assert len(q.statements) == 1
    with database.session() as s:
        assert [repo.cache_get(s, k) for k in "abcd"] == [b"new", b"\x01", b"", None]


def test_verify_signals_finds_a_changed_sample(writable_demo):
    from sqlalchemy import select, update

    from railval.db.models import Channel, Recording, Section, Signal

    with writable_demo.session(write=True) as s:
        assert repo.verify_signals(s, "demo") == []
        assert len(repo.load_signalsets(s, "demo", sections=["S03"], verify=True)) == 1
        sig_id = s.scalar(
            select(Signal.id).join(Recording).join(Section).join(Channel)
            .where(Section.section_id == "S03", Recording.configuration_id.is_(None),
                   Channel.name == "Q_w1R"))
        values = repo.load_signalsets(s, "demo", sections=["S03"])["S03"].channels["Q_w1R"]
        values[100] += 1e-9  # a tampered sample, re-encoded with the old hash kept
        s.execute(update(Signal).where(Signal.id == sig_id).values(blob=codec.encode(values)[0]))
    with writable_demo.session() as s:
        problems = repo.verify_signals(s, "demo")
        assert [(p["section"], p["configuration"], p["channel"]) for p in problems] == [
            ("S03", None, "Q_w1R")]
        assert "differs from the expected" in problems[0]["error"]
        with pytest.raises(InvalidSignal, match="differs from the expected"):
            repo.load_signalsets(s, "demo", sections=["S03"], verify=True)


def test_references_resolved_once_need_no_further_lookup(demo):
    """docs/design.md §2: a request resolves campaign and configuration once; given the
    references, each repository read is exactly its own query (no name lookup), and gives what
    the names give."""
    with demo.session() as s:
        camp, conf = repo.resolve(s, "demo", "variant1")
        assert (camp.name, conf.name, conf.campaign) == ("demo", "variant1", camp)
        by_name = repo.signal_hashes(s, "demo", "variant1")
        by_ref = {}
        for name, call in (("signal_hashes", lambda: repo.signal_hashes(s, camp, conf)),
                           ("recording_meta", lambda: repo.recording_meta(s, camp, conf)),
                           ("fetch_signalsets", lambda: repo.fetch_signalsets(s, camp, conf, ["S03"])),
                           ("list_configurations", lambda: repo.list_configurations(s, camp))):
            with QueryCounter(demo.engine) as q:
                by_ref[name] = call()
            assert len(q.statements) == 1, (name, q.statements)
            assert all("configuration.name =" not in x and "campaign.name =" not in x
                       for x in q.statements), name
        assert by_ref["signal_hashes"] == by_name
        assert repo.recording_meta(s, "demo", "variant1") == by_ref["recording_meta"]
        assert list(by_ref["fetch_signalsets"]()) == ["S03"]
        assert [c.name for c in repo.lineage(s, camp, conf)] == ["baseline", "variant1"]
        assert repo.resolve(s, camp, conf) == (camp, conf)
        with pytest.raises(NotFound, match="'nope' not found in campaign 'demo'"):
            repo.resolve(s, camp, "nope")


def test_a_reference_to_a_deleted_configuration_is_not_found(writable_demo):
    with writable_demo.session(write=True) as s:
        camp, conf = repo.resolve(s, "demo", "variant1")
        repo.delete_configuration(s, camp, conf)
    with writable_demo.session() as s:
        with pytest.raises(NotFound, match="configuration 'variant1' of campaign 'demo' no longer exists"):
            repo.get_configuration(s, camp, conf)
        with pytest.raises(NotFound, match="'variant1' not found in campaign 'demo'"):
            repo.get_configuration(s, camp, "variant1")


def test_repo_namespace_keeps_every_name_its_callers_use():
    """``from railval.db import repo; repo.X`` for every X the repository's modules define; the
    storage check has one name (``verify_storage``; ``verify_database`` is the audit service's)."""
    from railval.db import cache, campaigns, configurations, seals, signals

    for module in (cache, campaigns, configurations, seals, signals):
        public = [n for n, v in vars(module).items() if callable(v) and not n.startswith("_")
                  and getattr(v, "__module__", "") == module.__name__]
        assert public and all(getattr(repo, n) is getattr(module, n) for n in public), module.__name__
    assert not hasattr(repo, "verify_database")
    assert all(hasattr(repo, n) for n in repo.__all__)
