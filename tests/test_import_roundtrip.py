"""Import → export → import reproduces identical content hashes, in every file format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railval.db import codec, repo
from railval.db.exporter import export_campaign
from railval.db.importer import STANDARD_GRAVITY, import_campaign
from railval.db.io import read_table, write_table
from tests.factories import CHANNELS, write_demo_campaign


def _all_hashes(database, name):
    with database.session() as s:
        out = {"measured": repo.signal_hashes(s, name)}
        for c in repo.list_configurations(s, name):
            out[c.name] = repo.signal_hashes(s, name, c.name)
        return out


def _expected_hashes(folder):
    """Hashes computed straight from the files, independently of the database."""
    m = json.loads((folder / "campaign.json").read_text())
    out = {"measured": {}}
    for s in m["sections"]:
        cols = read_table(folder / s["measured"])
        out["measured"][s["id"]] = {ch: codec.content_hash(cols[ch]) for ch in CHANNELS if ch in cols}
    for c in m["configurations"]:
        out[c["name"]] = {}
        for sid, rel in c["files"].items():
            cols = read_table(folder / rel)
            out[c["name"]][sid] = {ch: codec.content_hash(cols[ch]) for ch in CHANNELS if ch in cols}
    return out


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_round_trip_both_backends(database, tmp_path, fmt):
    src = tmp_path / "src"
    write_demo_campaign(src, n_sections=2, fmt="csv", n_configs=2, seed=3)
    assert import_campaign(database, src) == "demo"
    first = _all_hashes(database, "demo")
    assert first == _expected_hashes(src)
    with database.session() as s:
        export_campaign(s, "demo", tmp_path / "out", fmt=fmt)
        meta_before = (repo.section_infos(s, "demo"), repo.vehicle_info(s, "demo"),
                       [(c.name, c.parent_id is not None, c.parameters)
                        for c in repo.list_configurations(s, "demo")])
        measured = repo.load_signalsets(s, "demo")
    with database.session(write=True) as s:  # delete (cascades to every row of it), then re-import
        s.delete(repo.get_campaign(s, "demo"))
    with database.session() as s:  # the append-only audit trail keeps its rows: the
        counts = repo.row_counts(s)  # database's signed identity and the import
        assert (counts.pop("audit_event"), counts.pop("audit_head")) == (2, 1)
        assert sum(counts.values()) == 0
    target = database
    assert import_campaign(target, tmp_path / "out") == "demo"
    assert _all_hashes(target, "demo") == first
    with target.session() as s:
        assert (repo.section_infos(s, "demo"), repo.vehicle_info(s, "demo"),
                [(c.name, c.parent_id is not None, c.parameters)
                 for c in repo.list_configurations(s, "demo")]) == meta_before
        again = repo.load_signalsets(s, "demo")
    for sid, ss in measured.items():
        assert again[sid].fs == ss.fs
        assert np.array_equal(again[sid].time_s, ss.time_s)
        assert np.array_equal(again[sid].distance_m, ss.distance_m)


@pytest.mark.parametrize("fmt", ["h5", "mat", "mf4", "tdms"])
def test_every_format_imports_and_exports_exactly(sqlite_database, tmp_path, fmt):
    src = tmp_path / "src"
    write_demo_campaign(src, n_sections=2, fmt=fmt, seed=4)
    import_campaign(sqlite_database, src)
    first = _all_hashes(sqlite_database, "demo")
    assert first == _expected_hashes(src)
    with sqlite_database.session(write=True) as s:
        export_campaign(s, "demo", tmp_path / "out", fmt=fmt)
        s.delete(repo.get_campaign(s, "demo"))
    import_campaign(sqlite_database, tmp_path / "out")
    assert _all_hashes(sqlite_database, "demo") == first


def test_units_are_converted_and_recorded(sqlite_database, tmp_path):
    """Forces given in N and accelerations in g are stored in kN and m/s²."""
    src = tmp_path / "src"
    write_demo_campaign(src, n_sections=1, fmt="parquet", seed=8)
    m = json.loads((src / "campaign.json").read_text())
    reference = read_table(src / m["sections"][0]["measured"])
    for rel in [m["sections"][0]["measured"], *m["configurations"][0]["files"].values()]:
        cols = read_table(src / rel)
        for ch in CHANNELS:
            cols[ch] = cols[ch] * 1000.0 if ch[0] in "YQ" else cols[ch] / STANDARD_GRAVITY
        write_table(src / rel, cols)
    for ch in m["channels"]:
        ch["unit"] = "N" if ch["kind"] in ("Y", "Q") else "g"
    (src / "campaign.json").write_text(json.dumps(m))
    import_campaign(sqlite_database, src)
    with sqlite_database.session() as s:
        ss = repo.load_signalsets(s, "demo")["S01"]
        units = {c.name: c.unit for c in repo.channels(s, "demo")}
        from railval.db.models import Recording, Signal
        prov = {sig.channel.name: sig.provenance
                for sig in s.query(Signal).join(Recording).filter(Recording.configuration_id.is_(None))}
    assert units["Y_w1L"] == "kN" and units["ay_cb_b1"] == "m/s^2"
    for ch in CHANNELS:  # two float operations: a few ulp
        np.testing.assert_allclose(ss.channels[ch], reference[ch], rtol=1e-14, atol=1e-15)
    assert prov["Q_w2L"]["unit_conversion"] == {"from": "N", "to": "kN", "factor": 0.001}
    assert prov["az_cb_b2"]["unit_conversion"] == {"from": "g", "to": "m/s^2",
                                                   "factor": STANDARD_GRAVITY}
    assert prov["Q_w2L"]["file"] == "measured/S01.parquet"


def test_factory_campaign_is_physically_plausible(tmp_path):
    """Quasi-static ΣY of the leading wheelset ≈ 1.3·M·a_q/4 with a_q = v²/R − g·h/s."""
    write_demo_campaign(tmp_path, n_sections=4, fmt="parquet")
    m = json.loads((tmp_path / "campaign.json").read_text())
    sec = m["sections"][3]  # zone 4: R 300 m, cant 150 mm, 75 km/h
    assert (sec["radius_m"], sec["cant_mm"], sec["speed_kmh"]) == (300.0, 150.0, 75.0)
    cols = read_table(tmp_path / sec["measured"])
    d = cols["distance_m"]
    inside = (d >= sec["evaluated"]["start_m"]) & (d <= sec["evaluated"]["end_m"])
    v = 75 / 3.6
    a_q = v * v / 300 - 9.80665 * 0.150 / 1.5  # m/s², ≈ 0.466
    mass = 77.0 * 1000 * 8 / 9.80665
    sumy = (cols["Y_w1L"] + cols["Y_w1R"])[inside]
    expected = 1.3 * mass * a_q / 4 / 1000 * sec["curve_direction"]
    assert np.median(sumy) == pytest.approx(expected, rel=0.05)
    q = np.concatenate([cols[f"Q_{w}"][~inside] for w in ("w1L", "w1R", "w2L", "w2R")])
    assert np.median(q) == pytest.approx(77.0, abs=0.5)  # on the straight: Q0
    t = cols["time_s"]
    assert 26.0 <= t[-1] <= 40.0 and np.allclose(np.diff(t), 1 / 200.0)
